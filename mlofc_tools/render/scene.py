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
Static description of the synthetic scene: striped cuboids and a striped background wall.

Every body is a set of planar faces in its own body frame (units are arbitrary scene units,
the camera sits at the origin of the camera optical frame: x right, y down, z forward).
A face carries painted convex polygons (the face itself, stripe bands, band crossings) for
drawing, and the body carries the straight 3D edges (cube edges and stripe edges) that the
ground truth reports.  Poses follow ``X(t) = R(t) (X0 - P) + P`` with
``R(t) = exp([omega t]x)`` and pivot ``P``.
"""
from dataclasses import dataclass
import math
from typing import List, Optional, Sequence, Tuple

from mlofc_tools.render.geometry import (clip_convex_polygon, random_rotation, so3_exp,
                                         so3_exp_many)
import numpy as np

#: Multipliers of a face's albedo: plain face, band of direction 1, direction 2, crossing.
BOX_PATTERN = (1.0, 0.3, 0.6, 0.12)
#: Background wall: base grey and the multipliers of its grid of bands.
BACKGROUND_GREY = 70.0
BACKGROUND_PATTERN = (1.0, 2.0, 1.5, 2.8)


@dataclass
class Body:
    """
    One rigid body: geometry in its body frame plus its motion.

    Attributes (``Nv`` polygon vertices, ``Np`` polygons, ``Nf`` faces, ``Ne`` edges):
      name: ``'background'`` or ``'box<i>'``.
      rot0: (3, 3) body-to-camera rotation at t = 0.
      centre0: (3,) body origin in the camera frame at t = 0 (scene units).
      omega: (3,) angular velocity, rad/s, camera frame.
      pivot: (3,) camera-frame pivot of the rotation (origin or the body centre).
      verts: (Nv, 3) polygon vertices, body frame, polygons stored consecutively.
      poly_start: (Np + 1,) start index of every polygon in ``verts``.
      poly_face: (Np,) local face index of every polygon (polygons drawn in this order).
      poly_grey: (Np,) grey level of every polygon (0..255).
      vert_next: (Nv,) index of the next vertex of the same polygon (edge i -> next[i]).
      vert_other_face: (Nv,) local index of the face across polygon edge ``i -> next[i]`` when
        that edge lies on a cube edge, else -1 (used for seam-free anti-aliasing).
      face_normal, face_point: (Nf, 3) outward normal and a point of every face, body frame.
      face_rect: (Nf, 4, 3) the face outline (used for the face-id buffer), body frame.
      edge_a, edge_b: (Ne, 3) endpoints of the straight 3D edges, body frame.
      edge_faces: (Ne, 2) local faces adjacent to each edge (second is -1 for stripe edges).
      radius: bounding-sphere radius about the body origin (scene units).
    """

    name: str
    rot0: np.ndarray
    centre0: np.ndarray
    omega: np.ndarray
    pivot: np.ndarray
    verts: np.ndarray
    poly_start: np.ndarray
    poly_face: np.ndarray
    poly_grey: np.ndarray
    vert_next: np.ndarray
    vert_other_face: np.ndarray
    face_normal: np.ndarray
    face_point: np.ndarray
    face_rect: np.ndarray
    edge_a: np.ndarray
    edge_b: np.ndarray
    edge_faces: np.ndarray
    radius: float

    def pose(self, t: float) -> Tuple[np.ndarray, np.ndarray]:
        """Body-to-camera ``(R (3, 3), centre (3,))`` at time ``t`` seconds."""
        rot = so3_exp(self.omega * t)
        centre = rot @ (self.centre0 - self.pivot) + self.pivot
        return rot @ self.rot0, centre


class _FaceBuilder:
    """Accumulates faces, painted polygons and edges of one body (body frame)."""

    def __init__(self) -> None:
        self.polys: List[np.ndarray] = []
        self.poly_face: List[int] = []
        self.poly_grey: List[float] = []
        self.poly_other: List[np.ndarray] = []
        self.face_normal: List[np.ndarray] = []
        self.face_point: List[np.ndarray] = []
        self.face_rect: List[np.ndarray] = []
        self.edges: List[Tuple[np.ndarray, np.ndarray, int, int]] = []

    def add_face(self, origin: np.ndarray, ax_s: np.ndarray, ax_t: np.ndarray,
                 normal: np.ndarray, half: Tuple[float, float], grey: float,
                 pattern: Sequence[float], bands: Sequence[Tuple[np.ndarray, List[float]]],
                 side_faces: Optional[Sequence[int]] = None) -> int:
        """
        Add a rectangular face ``origin + s ax_s + t ax_t``, ``|s| <= half[0], |t| <= half[1]``.

        ``bands``: per stripe direction a unit 2D normal ``n`` (in (s, t)) and sorted band
        boundaries ``[b0, b1, b2, b3, ...]`` (bands are ``b0 <= n.x <= b1`` etc.).
        ``side_faces``: the faces across the rectangle sides s=+h, t=+h, s=-h, t=-h (or None).
        Returns the local face index.
        """
        f = len(self.face_normal)
        hs, ht = half
        rect = np.array([[-hs, -ht], [hs, -ht], [hs, ht], [-hs, ht]], dtype=float)

        def to3d(p2: np.ndarray) -> np.ndarray:
            return origin + p2[:, :1] * ax_s + p2[:, 1:2] * ax_t

        def other_of(p2: np.ndarray) -> np.ndarray:
            # face across polygon edge i -> i+1 when the edge lies on the rectangle outline
            out = np.full(len(p2), -1, dtype=np.int64)
            if side_faces is None:
                return out
            q = np.roll(p2, -1, axis=0)
            tol = 1e-9 * max(hs, ht) + 1e-12
            for k, (axis, val) in enumerate(((0, hs), (1, ht), (0, -hs), (1, -ht))):
                on = (np.abs(p2[:, axis] - val) < tol) & (np.abs(q[:, axis] - val) < tol)
                out[on] = side_faces[k]
            return out

        def add_poly(p2: np.ndarray, g: float) -> None:
            if len(p2) < 3:
                return
            self.polys.append(to3d(p2))
            self.poly_face.append(f)
            self.poly_grey.append(float(np.clip(g, 0.0, 255.0)))
            self.poly_other.append(other_of(p2))

        add_poly(rect, grey * pattern[0])
        strips = []
        for n2, bounds in bands:
            strips.append([(n2, bounds[i], bounds[i + 1]) for i in range(0, len(bounds) - 1, 2)])
            for b in bounds:       # stripe edges: the line n.x = b inside the rectangle
                half_plane = clip_convex_polygon(rect, n2, b)
                on = np.abs(half_plane @ n2 - b) < 1e-9 * max(hs, ht) + 1e-12
                pts = half_plane[on]
                if len(pts) >= 2:
                    a3 = to3d(pts[:1])[0]
                    b3 = to3d(pts[-1:])[0]
                    if np.linalg.norm(a3 - b3) > 1e-6:
                        self.edges.append((a3, b3, f, -1))
        for d, bands_d in enumerate(strips):
            for n2, lo, hi in bands_d:
                poly = clip_convex_polygon(clip_convex_polygon(rect, n2, hi), -n2, -lo)
                add_poly(poly, grey * pattern[1 + d])
        if len(strips) == 2:
            for n1, lo1, hi1 in strips[0]:
                for n2, lo2, hi2 in strips[1]:
                    poly = clip_convex_polygon(rect, n1, hi1)
                    poly = clip_convex_polygon(poly, -n1, -lo1)
                    poly = clip_convex_polygon(poly, n2, hi2)
                    poly = clip_convex_polygon(poly, -n2, -lo2)
                    add_poly(poly, grey * pattern[3])
        self.face_normal.append(np.asarray(normal, dtype=float))
        self.face_point.append(np.asarray(origin, dtype=float))
        self.face_rect.append(to3d(rect))
        return f

    def build(self, name: str, radius: float) -> Body:
        """Freeze into a :class:`Body` with identity pose and zero motion."""
        sizes = np.array([len(p) for p in self.polys], dtype=np.int64)
        start = np.concatenate([[0], np.cumsum(sizes)])
        idx = np.arange(start[-1])
        first = np.repeat(start[:-1], sizes)
        last = np.repeat(start[1:] - 1, sizes)
        nxt = np.where(idx == last, first, idx + 1)
        if self.edges:
            ea = np.array([e[0] for e in self.edges])
            eb = np.array([e[1] for e in self.edges])
            ef = np.array([[e[2], e[3]] for e in self.edges], dtype=np.int64)
        else:
            ea = eb = np.zeros((0, 3))
            ef = np.zeros((0, 2), dtype=np.int64)
        return Body(
            name=name, rot0=np.eye(3), centre0=np.zeros(3), omega=np.zeros(3),
            pivot=np.zeros(3), verts=np.concatenate(self.polys), poly_start=start,
            poly_face=np.array(self.poly_face, dtype=np.int64),
            poly_grey=np.array(self.poly_grey), vert_next=nxt,
            vert_other_face=np.concatenate(self.poly_other),
            face_normal=np.array(self.face_normal), face_point=np.array(self.face_point),
            face_rect=np.array(self.face_rect), edge_a=ea, edge_b=eb, edge_faces=ef,
            radius=float(radius))


def _random_bands(rng: np.random.Generator, n2: np.ndarray, half: Tuple[float, float],
                  n_bands: int, span: float = 0.8) -> List[float]:
    """Sorted boundaries of ``n_bands`` bands across ``|n2 . x| <= span * r`` of a rectangle."""
    r = abs(n2[0]) * half[0] + abs(n2[1]) * half[1]
    w = rng.uniform(0.6, 1.4, 2 * n_bands + 1)
    cuts = np.cumsum(w)[:-1] / w.sum()
    return list((2.0 * cuts - 1.0) * span * r)


def make_box(rng: np.random.Generator, half: np.ndarray, name: str) -> Body:
    """
    Cuboid with half extents ``half`` (3,), centred on its body origin, with striped faces.

    The six faces get distinct albedos (so box edges have contrast) and 1 or 2 stripe
    directions each (3-4 bands for one direction, 2-3 bands per direction for two).
    """
    fb = _FaceBuilder()
    greys = rng.permutation(np.linspace(125.0, 245.0, 6)) + rng.uniform(-4, 4, 6)
    eye = np.eye(3)
    # face index of (axis, sign): 2 * axis + (0 if sign > 0 else 1)
    face_of = {(k, s): 2 * k + (0 if s > 0 else 1) for k in range(3) for s in (1, -1)}
    for k in range(3):
        i, j = (k + 1) % 3, (k + 2) % 3
        for s in (1, -1):
            n_dir = int(rng.integers(1, 3))
            phi = rng.uniform(0, math.pi)
            bands = []
            for d in range(n_dir):
                ang = phi + (d * rng.uniform(math.radians(50), math.radians(130)))
                n2 = np.array([math.cos(ang), math.sin(ang)])
                nb = int(rng.integers(3, 5)) if n_dir == 1 else int(rng.integers(2, 4))
                bands.append((n2, _random_bands(rng, n2, (half[i], half[j]), nb)))
            sides = [face_of[(i, 1)], face_of[(j, 1)], face_of[(i, -1)], face_of[(j, -1)]]
            fb.add_face(s * half[k] * eye[k], eye[i], eye[j], s * eye[k], (half[i], half[j]),
                        greys[face_of[(k, s)]], BOX_PATTERN, bands, sides)
    # the 12 cube edges: along axis a, at signs (s1, s2) of the two other axes
    for a in range(3):
        b, c = (a + 1) % 3, (a + 2) % 3
        for s1 in (1, -1):
            for s2 in (1, -1):
                p = s1 * half[b] * eye[b] + s2 * half[c] * eye[c]
                fb.edges.append((p - half[a] * eye[a], p + half[a] * eye[a],
                                 face_of[(b, s1)], face_of[(c, s2)]))
    return fb.build(name, float(np.linalg.norm(half)))


def make_background(rng: np.random.Generator, K: np.ndarray,
                    canvas: Tuple[int, int, int, int], depth: float = 12.0) -> Body:
    """
    Build a static wall at ``depth`` (slightly tilted) covering the canvas, with band grid.

    ``canvas = (u0, v0, width, height)`` in image pixels (the region that is rasterised).
    """
    tilt = so3_exp(rng.uniform(-1, 1, 3) * np.array([0.15, 0.15, 0.1]))
    centre = np.array([0.0, 0.0, depth])
    u0, v0, wc, hc = canvas
    corners = np.array([[u0, v0], [u0 + wc, v0], [u0 + wc, v0 + hc], [u0, v0 + hc]], float)
    rays = np.c_[corners, np.ones(4)] @ np.linalg.inv(K).T
    normal_cam = tilt @ np.array([0.0, 0.0, -1.0])
    lam = (normal_cam @ centre) / (rays @ normal_cam)
    pts_body = (lam[:, None] * rays - centre) @ tilt   # into the body frame (plane z = 0)
    hs = 1.2 * float(np.abs(pts_body[:, 0]).max())
    ht = 1.2 * float(np.abs(pts_body[:, 1]).max())
    fb = _FaceBuilder()
    bands = []
    for d in range(2):
        ang = d * math.pi / 2 + rng.uniform(-0.2, 0.2)
        n2 = np.array([math.cos(ang), math.sin(ang)])
        bands.append((n2, _random_bands(rng, n2, (hs / 1.2, ht / 1.2), int(rng.integers(3, 5)),
                                        span=0.75)))
    fb.add_face(np.zeros(3), np.array([1.0, 0, 0]), np.array([0, 1.0, 0]),
                np.array([0, 0, -1.0]), (hs, ht), BACKGROUND_GREY, BACKGROUND_PATTERN, bands)
    body = fb.build('background', math.hypot(hs, ht))
    body.rot0 = tilt
    body.centre0 = centre
    body.pivot = centre.copy()
    return body


def _cells(n: int, width: int, height: int) -> List[Tuple[float, float, float, float]]:
    """Image cells ``(u_centre, v_centre, cell_w, cell_h)`` of a layout of ``n`` boxes."""
    w, h = float(width), float(height)
    if n == 1:
        return [(w / 2, h / 2, w, h)]
    if n == 2:
        return [(w / 4, h / 2, w / 2, h), (3 * w / 4, h / 2, w / 2, h)]
    if n == 3:
        return [(w / 4, h / 4, w / 2, h / 2), (3 * w / 4, h / 4, w / 2, h / 2),
                (w / 2, 3 * h / 4, w / 2, h / 2)]
    return [(w / 4, h / 4, w / 2, h / 2), (3 * w / 4, h / 4, w / 2, h / 2),
            (w / 4, 3 * h / 4, w / 2, h / 2), (3 * w / 4, 3 * h / 4, w / 2, h / 2)]


def _cone_axis(rng: np.random.Generator, centre: np.ndarray, max_angle: float) -> np.ndarray:
    """Random unit axis within ``max_angle`` rad of ``+-centre`` (uniform on the caps)."""
    z = centre / np.linalg.norm(centre)
    cos_t = rng.uniform(math.cos(max_angle), 1.0)
    psi = rng.uniform(0, 2 * math.pi)
    tmp = np.array([1.0, 0, 0]) if abs(z[0]) < 0.9 else np.array([0, 1.0, 0])
    x = np.cross(z, tmp)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    sin_t = math.sqrt(max(0.0, 1 - cos_t ** 2))
    axis = cos_t * z + sin_t * (math.cos(psi) * x + math.sin(psi) * y)
    return axis if rng.uniform() < 0.5 else -axis


def place_boxes(rng: np.random.Generator, n_boxes: int, size: Tuple[int, int], K: np.ndarray,
                motion: str, stamps: np.ndarray, speed_range: Tuple[float, float],
                depth_range: Tuple[float, float] = (4.0, 8.0)) -> List[Body]:
    """
    Sample ``n_boxes`` striped boxes and motions that stay in view and apart for all stamps.

    Boxes sit in a layout of image cells at a depth drawn from ``depth_range`` (scene units;
    a box's size follows from its image cell and depth); their bounding circles (projected
    bounding spheres) stay inside the image and overlap by at most ~10% of the radii sum in
    every frame.  For ``motion='camera_centre'`` the rotation moves the box across the image,
    so the axis is drawn in a cone about the box's mid-sequence line of sight that narrows
    with each rejected attempt (``own_centre`` boxes spin in place with a uniform axis).
    """
    width, height = size
    f = float(K[0, 0])
    kinv = np.linalg.inv(K)
    t_mid = 0.5 * (float(stamps[0]) + float(stamps[-1]))
    half_span = max(1e-9, 0.5 * (float(stamps[-1]) - float(stamps[0])))
    cells = _cells(n_boxes, width, height)
    lo, hi = (math.radians(x) for x in speed_range)
    n_attempts = 60
    for attempt in range(n_attempts + 1):
        final = attempt == n_attempts
        plans = []
        for uc, vc, cw, ch in cells:
            jit = 0.0 if final else 0.08
            u = uc + rng.uniform(-jit, jit) * cw
            v = vc + rng.uniform(-jit, jit) * ch
            r_px = rng.uniform(0.36, 0.46) * min(cw, ch)
            z = rng.uniform(*depth_range)
            c_mid = z * (kinv @ np.array([u, v, 1.0]))
            speed = rng.uniform(lo, hi)
            if motion == 'own_centre':
                axis = rng.standard_normal(3)
                axis /= np.linalg.norm(axis)
                omega = speed * axis
                centre0, pivot = c_mid, c_mid.copy()
            else:
                drift = 0.35 * min(cw, ch) * 3.0 * 0.93 ** attempt / f   # rad of allowed drift
                s = drift / max(speed * half_span, 1e-12)
                max_angle = 0.0 if final else (math.pi / 2 if s >= 1 else math.asin(s))
                omega = speed * _cone_axis(rng, c_mid, max_angle)
                centre0, pivot = so3_exp(-omega * t_mid) @ c_mid, np.zeros(3)
            plans.append((centre0, pivot, omega, r_px * z / f))
        if final or _layout_ok(plans, stamps, K, size):
            break
    boxes = []
    for b, (centre0, pivot, omega, radius) in enumerate(plans):
        shape = rng.uniform(0.45, 1.0, 3)
        box = make_box(rng, radius * shape / np.linalg.norm(shape), f'box{b}')
        box.centre0, box.pivot, box.omega = centre0, pivot, omega
        # orientation at t = 0 that shows three faces (for >= 20 edges in frame 0)
        view = -centre0 / np.linalg.norm(centre0)
        for _ in range(200):
            rot = random_rotation(rng)
            if np.all(np.abs(rot.T @ view) > 0.3):
                break
        box.rot0 = rot
        boxes.append(box)
    return boxes


def _layout_ok(plans: List[Tuple[np.ndarray, np.ndarray, np.ndarray, float]],
               stamps: np.ndarray, K: np.ndarray, size: Tuple[int, int]) -> bool:
    """
    Check that every planned box stays in view and the boxes stay apart at every stamp.

    ``plans``: per box ``(centre0 (3,), pivot (3,), omega (3,) rad/s, radius)``.
    """
    width, height = size
    f = float(K[0, 0])
    cen = np.empty((len(plans), len(stamps), 2))
    rad = np.empty((len(plans), len(stamps)))
    for b, (centre0, pivot, omega, radius) in enumerate(plans):
        rots = so3_exp_many(np.outer(stamps, omega))
        c = rots @ (centre0 - pivot) + pivot                 # (F, 3)
        if np.any(c[:, 2] < radius + 1.0):
            return False
        p = c @ K.T
        cen[b] = p[:, :2] / p[:, 2:]
        rad[b] = f * radius / c[:, 2]
    m = 0.6 * rad
    if np.any(cen[..., 0] < m) or np.any(cen[..., 0] > width - 1 - m):
        return False
    if np.any(cen[..., 1] < m) or np.any(cen[..., 1] > height - 1 - m):
        return False
    for a in range(len(plans)):
        for b in range(a + 1, len(plans)):
            dist = np.linalg.norm(cen[a] - cen[b], axis=1)
            if np.any(dist < 0.9 * (rad[a] + rad[b])):
                return False
    return True
