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

"""Synthetic renderer: API, determinism, ground truth on image edges, motion, distortion."""
import math

import cv2
from mlofc_ros.camera import CameraModel
from mlofc_tools.render import FrameTruth, render_sequence, RenderedSequence
from mlofc_tools.render.geometry import distort_pixels, so3_exp
import numpy as np
import pytest

DIST = (-0.28, 0.09, 0.001, -0.0015, -0.01)


@pytest.fixture(scope='module')
def seq() -> RenderedSequence:
    return render_sequence(n_boxes=2, n_frames=20, seed=0)


@pytest.fixture(scope='module')
def seq_own() -> RenderedSequence:
    return render_sequence(n_boxes=3, n_frames=12, motion='own_centre', seed=5)


@pytest.fixture(scope='module')
def seq_dist() -> RenderedSequence:
    return render_sequence(n_boxes=2, n_frames=2, noise_sigma=0.0, seed=2, distortion=DIST)


def _gradient(img: np.ndarray) -> np.ndarray:
    g = img.astype(np.float32)
    return cv2.magnitude(cv2.Sobel(g, cv2.CV_32F, 1, 0, ksize=3) / 8,
                         cv2.Sobel(g, cv2.CV_32F, 0, 1, ksize=3) / 8)


def _sample(img: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """Bilinear samples of a float image at pixels pts (N, 2)."""
    p = pts.astype(np.float32).reshape(-1, 1, 2)
    return cv2.remap(img, p[..., 0], p[..., 1], cv2.INTER_LINEAR).ravel()


def _points_along(segs: np.ndarray, step: float = 1.0, margin: float = 3.0) -> np.ndarray:
    out = []
    for s in segs:
        p, q = s[:2], s[2:]
        n = np.linalg.norm(q - p)
        t = np.arange(margin, n - margin, step) / n
        out.append(p + t[:, None] * (q - p))
    return np.concatenate(out)


def _normals(seg: np.ndarray, K: np.ndarray) -> np.ndarray:
    """Return unit interpretation-plane normals m = K^-1 p1 x K^-1 p2 of segments (N, 4)."""
    kinv = np.linalg.inv(K)
    a = np.c_[seg[:, :2], np.ones(len(seg))] @ kinv.T
    b = np.c_[seg[:, 2:], np.ones(len(seg))] @ kinv.T
    m = np.cross(a, b)
    return m / np.linalg.norm(m, axis=1)[:, None]


def test_api_shapes(seq):
    assert len(seq.frames) == 20 and len(seq.truth) == 20
    assert all(f.shape == (480, 640) and f.dtype == np.uint8 for f in seq.frames)
    np.testing.assert_allclose(seq.stamps, np.arange(20) / 30.0)
    assert isinstance(seq.camera, CameraModel)
    assert seq.camera.fx == seq.camera.fy == pytest.approx(0.9 * 640)
    assert not seq.camera.has_distortion and seq.pinhole_frames is None
    assert seq.body_names == ['background', 'box0', 'box1']
    w = seq.angular_velocities
    assert w.shape == (3, 3) and w.dtype == np.float64
    assert np.all(w[0] == 0)
    speed = np.degrees(np.linalg.norm(w[1:], axis=1))
    assert np.all((speed >= 60 - 1e-9) & (speed <= 150 + 1e-9))
    for tr in seq.truth:
        assert isinstance(tr, FrameTruth)
        n = len(tr.segments)
        assert tr.segments.shape == (n, 4) and tr.segments_distorted.shape == (n, 4)
        np.testing.assert_array_equal(tr.segments, tr.segments_distorted)
        assert tr.body_ids.shape == tr.edge_ids.shape == tr.visible_fraction.shape == (n,)
        assert len(np.unique(tr.edge_ids)) == n
        assert np.all((tr.visible_fraction > 0) & (tr.visible_fraction <= 1))
        assert np.all(tr.segments[:, 0::2] >= 0) and np.all(tr.segments[:, 0::2] <= 639)
        assert np.all(tr.segments[:, 1::2] >= 0) and np.all(tr.segments[:, 1::2] <= 479)
    # an edge id always belongs to the same body
    ids = np.concatenate([tr.edge_ids for tr in seq.truth])
    bodies = np.concatenate([tr.body_ids for tr in seq.truth])
    for e in np.unique(ids):
        assert len(np.unique(bodies[ids == e])) == 1


def test_deterministic(seq):
    again = render_sequence(n_boxes=2, n_frames=20, seed=0)
    assert all(np.array_equal(a, b) for a, b in zip(seq.frames, again.frames))
    np.testing.assert_array_equal(seq.angular_velocities, again.angular_velocities)
    for a, b in zip(seq.truth, again.truth):
        np.testing.assert_array_equal(a.segments, b.segments)
        np.testing.assert_array_equal(a.edge_ids, b.edge_ids)
    other = render_sequence(n_boxes=2, n_frames=2, seed=1)
    assert not np.array_equal(other.frames[0], seq.frames[0])


@pytest.mark.parametrize('n_boxes,motion,seed', [
    (1, 'camera_centre', 3), (2, 'own_centre', 4), (3, 'camera_centre', 6),
    (4, 'camera_centre', 7), (4, 'own_centre', 8)])
def test_every_box_has_20_segments(n_boxes, motion, seed):
    s = render_sequence(n_boxes=n_boxes, n_frames=10, motion=motion, seed=seed)
    assert len(s.body_names) == n_boxes + 1
    counts = np.bincount(s.truth[0].body_ids, minlength=n_boxes + 1)
    assert np.all(counts[1:] >= 20), counts
    assert counts[0] >= 4, counts     # the background shows its bands too


def test_noise_level():
    clean = render_sequence(n_boxes=1, n_frames=1, seed=9, noise_sigma=0.0).frames[0]
    noisy = render_sequence(n_boxes=1, n_frames=1, seed=9, noise_sigma=3.0).frames[0]
    diff = noisy.astype(float) - clean
    assert abs(diff.mean()) < 0.1 and diff.std() == pytest.approx(3.0, rel=0.1)


def test_segments_on_strong_edges(seq, seq_own):
    rng = np.random.default_rng(0)
    for s, frame in ((seq, 0), (seq, 19), (seq_own, 11)):
        tr = s.truth[frame]
        grad = _gradient(s.frames[frame])
        long = tr.segments[np.hypot(tr.segments[:, 2] - tr.segments[:, 0],
                                    tr.segments[:, 3] - tr.segments[:, 1]) >= 30]
        assert len(long) >= 20
        on_edges = _sample(grad, _points_along(long))
        rand = _sample(grad, rng.uniform([0, 0], [639, 479], (5000, 2)))
        assert on_edges.mean() > 4 * rand.mean(), (on_edges.mean(), rand.mean())
        # and edge by edge: nearly every long segment is a real edge along its length
        per_seg = [_sample(grad, _points_along(x[None])).mean() for x in long]
        assert np.mean(np.array(per_seg) > 2 * rand.mean()) > 0.9


def test_segments_subpixel_accurate():
    """The gradient centroid across a GT edge lies on the GT line (noise-free frame)."""
    s = render_sequence(n_boxes=2, n_frames=1, seed=11, noise_sigma=0.0)
    img = s.frames[0].astype(np.float32)
    offs = np.arange(-2.0, 2.01, 0.25)
    errors = []
    for seg in s.truth[0].segments:
        p, q = seg[:2], seg[2:]
        n_len = np.linalg.norm(q - p)
        if n_len < 40:
            continue
        d = (q - p) / n_len
        nrm = np.array([-d[1], d[0]])
        t = np.linspace(6, n_len - 6, int(n_len / 4))
        pts = p + t[:, None, None] * d + offs[None, :, None] * nrm
        prof = _sample(img, pts.reshape(-1, 2)).reshape(len(t), len(offs)).mean(0)
        g = np.abs(np.diff(prof))
        if g.max() < 10:
            continue
        w = g * (g > 0.2 * g.max())
        errors.append(float((w * (offs[:-1] + 0.125)).sum() / w.sum()))
    errors = np.abs(errors)
    assert len(errors) >= 30
    assert np.median(errors) < 0.1 and np.mean(errors < 0.3) > 0.8, np.sort(errors)


def test_camera_centre_motion_rotates_normals(seq):
    """Pure rotation: interpretation-plane normals rotate as m' = R m (R = exp(omega dt))."""
    K = seq.camera.K
    dt = seq.stamps[1] - seq.stamps[0]
    checked = 0
    for f in (0, 9, 18):
        a, b = seq.truth[f], seq.truth[f + 1]
        common, ia, ib = np.intersect1d(a.edge_ids, b.edge_ids, return_indices=True)
        m0 = _normals(a.segments[ia], K)
        m1 = _normals(b.segments[ib], K)
        for body in range(len(seq.body_names)):
            sel = a.body_ids[ia] == body
            R = so3_exp(seq.angular_velocities[body] * dt)
            pred = m0[sel] @ R.T
            err = np.linalg.norm(np.cross(pred, m1[sel]), axis=1)
            assert np.all(err < 1e-6), err.max()
            # a wrong rotation (another body's) does not fit the boxes
            if body > 0:
                wrong = so3_exp(seq.angular_velocities[3 - body] * dt)
                err_w = np.linalg.norm(np.cross(m0[sel] @ wrong.T, m1[sel]), axis=1)
                assert np.median(err_w) > 100 * max(err.max(), 1e-9)
            checked += sel.sum()
    assert checked > 150


def test_camera_centre_motion_moves_body_point(seq):
    """A box's pivot-relative point (its centre) moves on the rotated ray in the image."""
    K = seq.camera.K
    for body in (1, 2):
        w = seq.angular_velocities[body]
        mids = []
        for f in (0, 19):
            tr = seq.truth[f]
            segs = tr.segments[tr.body_ids == body]
            mids.append(np.r_[segs.reshape(-1, 2).mean(0), 1.0])
        # the direction of the mean of the box's edge points follows R (roughly: visibility
        # changes which edges are seen, so allow a few degrees)
        ray0 = np.linalg.solve(K, mids[0])
        ray1 = np.linalg.solve(K, mids[1])
        pred = so3_exp(w * seq.stamps[19]) @ ray0
        cos = pred @ ray1 / np.linalg.norm(pred) / np.linalg.norm(ray1)
        assert math.degrees(math.acos(min(1.0, cos))) < 4.0


def test_own_centre_motion(seq_own):
    """Boxes spin in place: the pivot is the box centre; lines also translate (m' != R m)."""
    K = seq_own.camera.K
    dt = seq_own.stamps[1]
    assert seq_own.body_names[0] == 'background'
    for body in range(1, len(seq_own.body_names)):
        pivot = seq_own.pivots[body]
        c = K @ pivot
        c = c[:2] / c[2]
        for tr in seq_own.truth:
            pts = tr.segments[tr.body_ids == body].reshape(-1, 2)
            assert np.linalg.norm(pts.mean(0) - c) < 60
        a, b = seq_own.truth[0], seq_own.truth[1]
        common, ia, ib = np.intersect1d(a.edge_ids, b.edge_ids, return_indices=True)
        sel = a.body_ids[ia] == body
        R = so3_exp(seq_own.angular_velocities[body] * dt)
        err = np.linalg.norm(np.cross(_normals(a.segments[ia][sel], K) @ R.T,
                                      _normals(b.segments[ib][sel], K)), axis=1)
        assert np.median(err) > 1e-4


def test_occluded_background_edges_are_cut(seq):
    """Background edges behind a box are reported partially (visible_fraction < 1)."""
    tr = seq.truth[0]
    bg = tr.body_ids == 0
    assert np.any(tr.visible_fraction[bg] < 0.9)
    # no reported background point lies inside a box's drawn area: check with the boxes'
    # segments' convex hulls, shrunk a little
    pts = _points_along(tr.segments[bg], step=2.0)
    for body in (1, 2):
        hull = cv2.convexHull(tr.segments[tr.body_ids == body].reshape(-1, 2).astype(np.float32))
        inside = [cv2.pointPolygonTest(hull, (float(x), float(y)), True) > 3 for x, y in pts]
        assert not any(inside)


def test_distortion(seq_dist):
    s = seq_dist
    K = s.camera.K
    D = np.array(s.camera.d)
    assert s.camera.d == pytest.approx(DIST) and s.pinhole_frames is not None
    undist = cv2.undistort(s.frames[0], K, D)
    pin = s.pinhole_frames[0]
    core = (slice(20, -20), slice(20, -20))
    diff = np.abs(undist.astype(float) - pin)[core]
    raw = np.abs(s.frames[0].astype(float) - pin)[core]
    assert diff.mean() < 2.0 and raw.mean() > 3 * diff.mean(), (diff.mean(), raw.mean())
    # the distorted frame has no black border: the pinhole canvas covers it all
    assert s.frames[0].min() > 10
    tr = s.truth[0]
    pts = distort_pixels(tr.segments.reshape(-1, 2), K, DIST)
    np.testing.assert_allclose(tr.segments_distorted.reshape(-1, 2), pts)
    proj, _ = cv2.projectPoints(
        np.c_[tr.segments.reshape(-1, 2), np.ones(2 * len(tr.segments))] @ np.linalg.inv(K).T,
        np.zeros(3), np.zeros(3), K, D)
    np.testing.assert_allclose(proj.reshape(-1, 2), pts, atol=1e-6)
    # GT segments, bent by the distortion, lie on edges of the distorted frame
    grad = _gradient(s.frames[0])
    long = tr.segments[np.hypot(tr.segments[:, 2] - tr.segments[:, 0],
                                tr.segments[:, 3] - tr.segments[:, 1]) >= 30]
    on_edges = _sample(grad, distort_pixels(_points_along(long), K, DIST))
    rand = _sample(grad, np.random.default_rng(1).uniform([0, 0], [639, 479], (5000, 2)))
    assert on_edges.mean() > 4 * rand.mean()
    # every distorted GT endpoint lies in the image
    dseg = tr.segments_distorted
    assert np.all((dseg[:, 0::2] > -0.5) & (dseg[:, 0::2] < 639.5))
    assert np.all((dseg[:, 1::2] > -0.5) & (dseg[:, 1::2] < 479.5))


def test_custom_camera_and_size():
    cam = CameraModel(300.0, 310.0, 161.0, 118.0)
    s = render_sequence(n_boxes=1, n_frames=2, size=(320, 240), camera=cam, seed=4)
    assert s.frames[0].shape == (240, 320) and s.camera == cam
    assert np.bincount(s.truth[0].body_ids)[1] >= 20
    s2 = render_sequence(n_boxes=1, n_frames=1, size=(320, 240), background=False,
                         camera=(300.0, 300.0, 160.0, 120.0), seed=4)
    assert s2.body_names == ['box0'] and np.all(s2.truth[0].body_ids == 0)


@pytest.mark.parametrize('kwargs', [
    {'n_boxes': 0}, {'n_boxes': 5}, {'n_frames': 0}, {'motion': 'spin'}, {'fps': 0.0},
    {'noise_sigma': -1.0}, {'angular_speed_deg_s': (10.0, 5.0)}, {'size': (8, 8)},
    {'distortion': (0.1, 0.0)}, {'depth_range': (0.0, 4.0)}, {'depth_range': (5.0, 4.0)},
    {'depth_range': (4.0, 11.0)},
])
def test_invalid_arguments(kwargs):
    with pytest.raises(ValueError):
        render_sequence(**kwargs)


def test_depth_range_places_the_boxes():
    near = render_sequence(n_boxes=2, n_frames=1, size=(320, 240), background=False,
                           motion='own_centre', seed=3, depth_range=(2.0, 2.5))
    far = render_sequence(n_boxes=2, n_frames=1, size=(320, 240), background=False,
                          motion='own_centre', seed=3, depth_range=(7.5, 8.0))
    for seq, (lo, hi) in ((near, (2.0, 2.5)), (far, (7.5, 8.0))):
        depths = [float(np.asarray(c)[2]) for c in seq.pivots]
        assert all(lo <= z <= hi for z in depths), depths
        assert np.bincount(seq.truth[0].body_ids).min() >= 10      # both boxes in view
