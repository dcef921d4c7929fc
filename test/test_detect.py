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
"""LineDetector: finds rendered GT edges, drops short segments, merges collinear fragments."""
import cv2
from mlofc_ros.segments.bridge import HOUGH_BINS
from mlofc_ros.segments.detect import (bridge_crossings, LineDetector, merge_collinear,
                                       orient_by_polarity)
from mlofc_ros.segments.merge import rows_not_in
import numpy as np
import pytest


def _on_line(seg, gt, angle_deg=3.0, dist_px=2.0):
    """(len(gt),) bool: some segment lies on each GT segment (angle, distance, overlap)."""
    gd = gt[:, 2:] - gt[:, :2]
    gl = np.linalg.norm(gd, axis=1)
    gu = gd / gl[:, None]
    gn = np.stack([-gu[:, 1], gu[:, 0]], 1)
    hit = np.zeros(len(gt), bool)
    for s in seg.astype(np.float64):
        d = s[2:] - s[:2]
        u = d / np.linalg.norm(d)
        cos = np.abs(gu @ u)
        e1 = np.abs(np.einsum('ij,ij->i', s[:2] - gt[:, :2], gn))
        e2 = np.abs(np.einsum('ij,ij->i', s[2:] - gt[:, :2], gn))
        t1 = np.einsum('ij,ij->i', s[:2] - gt[:, :2], gu)
        t2 = np.einsum('ij,ij->i', s[2:] - gt[:, :2], gu)
        lo = np.clip(np.minimum(t1, t2), 0, gl)
        hi = np.clip(np.maximum(t1, t2), 0, gl)
        ok = (cos >= np.cos(np.deg2rad(angle_deg))) & (np.maximum(e1, e2) <= dist_px) \
            & ((hi - lo) >= 0.5 * np.linalg.norm(d))
        hit |= ok
    return hit


def test_detects_rendered_gt_edges():
    render = pytest.importorskip('mlofc_tools.render')
    seq = render.render_sequence(n_boxes=2, n_frames=1, size=(640, 480), seed=0)
    truth = seq.truth[0]
    det = LineDetector(min_length=20.0)
    seg = det.detect(seq.frames[0])
    assert seg.dtype == np.float32 and seg.ndim == 2 and seg.shape[1] == 4
    gl = np.linalg.norm(truth.segments[:, 2:] - truth.segments[:, :2], axis=1)
    # long, mostly visible GT edges (the GT segment is the longest visible part)
    sel = (gl >= 40) & (truth.visible_fraction >= 0.9)
    recall = _on_line(seg, truth.segments[sel]).mean()
    assert recall >= 0.9, recall
    assert np.all(np.linalg.norm(seg[:, 2:] - seg[:, :2], axis=1) >= 20.0)


def test_rejects_short_segments_and_keeps_long():
    img = np.full((240, 320), 40, np.uint8)
    cv2.rectangle(img, (60, 60), (260, 180), 200, -1)       # 200 x 120 px edges
    cv2.rectangle(img, (20, 200), (30, 230), 200, -1)       # 10 x 30 px blob
    img = cv2.GaussianBlur(img, (5, 5), 1.0)
    for min_length in (20.0, 40.0):
        seg = LineDetector(min_length=min_length).detect(img)
        length = np.linalg.norm(seg[:, 2:] - seg[:, :2], axis=1)
        assert np.all(length >= min_length)
        rect = np.array([[60, 60, 260, 60], [260, 60, 260, 180], [260, 180, 60, 180],
                         [60, 180, 60, 60]], float)
        assert _on_line(seg, rect, dist_px=1.0).all()
    # the blob's 11 px sides are gone with a 20 px floor, its 31 px sides stay
    seg = LineDetector(min_length=20.0).detect(img)
    blob = (seg[:, [0, 2]].max(1) < 45) & (seg[:, [1, 3]].min(1) > 190)
    assert blob.sum() == 2


def test_scaled_backends_locate_edges_subpixel():
    # a supersampled step edge at u = 100.25 and v = 120.75 (pixel centres at integers)
    big = np.full((480 * 8, 640 * 8), 50, np.uint8)
    big[int((120.75 + 0.5) * 8):int((300.5 + 0.5) * 8),
        int((100.25 + 0.5) * 8):int((400.5 + 0.5) * 8)] = 200
    img = cv2.resize(big, (640, 480), interpolation=cv2.INTER_AREA)
    for backend, scale in (('lsd', 0.8), ('lsd', 0.5), ('lsd_resize', 0.5)):
        seg = LineDetector(backend=backend, scale=scale).detect(img)
        vert = np.abs(seg[:, 0] - seg[:, 2]) < 1
        left = seg[vert & (seg[:, 0] < 200)]
        assert left.shape[0] == 1, (backend, scale, seg)
        assert abs(left[0, 0] - 100.25) < 0.25, (backend, scale, left)
        horiz = np.abs(seg[:, 1] - seg[:, 3]) < 1
        top = seg[horiz & (seg[:, 1] < 200)]
        assert abs(top[0, 1] - 120.75) < 0.25, (backend, scale, top)


def test_orientation_brighter_on_the_left():
    img = np.full((200, 200), 30, np.uint8)
    img[:, 100:] = 220                      # bright right half: vertical edge at u = 99.5
    seg = LineDetector(min_length=20.0).detect(img)
    assert seg.shape[0] == 1
    # walking along (du, dv), the left side (dv, -du) must be the bright one (u > 100)
    d = seg[0, 2:] - seg[0, :2]
    assert d[1] > 0                          # walking down the image (v down), left is +u
    flipped = orient_by_polarity(img, seg[:, [2, 3, 0, 1]])
    np.testing.assert_allclose(flipped, seg)


def test_merge_joins_collinear_fragments():
    frags = np.array([[0, 0, 50, 0.2], [55, 0.3, 100, 0.4], [103, 0.5, 140, 0.6],
                      [0, 10, 50, 10],              # parallel, 10 px away: separate
                      [60, 20, 60, 80],             # perpendicular: separate
                      [200, 0.5, 240, 0.5]],        # collinear but 60 px gap: separate
                     np.float32)
    out = merge_collinear(frags, gap_px=10.0)
    assert out.shape == (4, 4)
    long_ = out[np.argmax(np.linalg.norm(out[:, 2:] - out[:, :2], axis=1))]
    assert long_[0] == pytest.approx(0.0, abs=0.3) and long_[2] == pytest.approx(140, abs=0.3)
    assert abs(long_[1]) < 0.3 and abs(long_[3] - 0.6) < 0.3


def test_merge_orientation_and_short_fragments():
    # opposite polarity pieces of one line (e.g. stripes crossing it) join unless oriented
    frags = np.array([[0, 0, 40, 0], [80, 0, 45, 0]], np.float32)
    assert merge_collinear(frags).shape == (1, 4)
    assert merge_collinear(frags, oriented=True).shape == (2, 4)
    merged = merge_collinear(np.array([[0, 0, 40, 0], [70, 0, 45, 0], [50, 0, 30, 0]],
                                      np.float32))
    assert merged.shape == (1, 4)
    assert merged[0, 0] > merged[0, 2]       # majority (by length) runs right to left
    # short noisy fragments along one line (angles differ by > 2 deg) still join
    frags = np.array([[458.5, 46.9, 476.5, 45.6], [478.5, 45.2, 489.5, 44.8],
                      [495.5, 44.1, 513.5, 42.7]], np.float32)
    assert merge_collinear(frags).shape == (1, 4)


def test_merge_is_vectorised_for_many_segments():
    rng = np.random.default_rng(1)
    p = rng.uniform(0, 600, (600, 2))
    a = rng.uniform(0, np.pi, 600)
    seg = np.c_[p, p + 15 * np.c_[np.cos(a), np.sin(a)]].astype(np.float32)
    out = merge_collinear(seg)
    assert 0 < out.shape[0] <= 600


def test_bad_input_raises():
    det = LineDetector()
    with pytest.raises(ValueError):
        det.detect(np.zeros((10, 10, 3), np.uint8))
    with pytest.raises(ValueError):
        det.detect(np.zeros((10, 10), np.float32))
    with pytest.raises(ValueError):
        LineDetector(scale=0.0)
    with pytest.raises(ValueError):
        LineDetector(backend='nope')
    with pytest.raises(ValueError):
        LineDetector(lsd_bins=0)


def test_coarse_lsd_bins_find_the_same_edges():
    # LSD seeds regions in the order of its gradient-norm bins; 32 bins instead of OpenCV's
    # 1024 (the default) only reorder seeds of about the same strength (the sort of every
    # pixel is most of LSD's time on a noisy image)
    render = pytest.importorskip('mlofc_tools.render')
    seq = render.render_sequence(n_boxes=3, n_frames=1, size=(640, 480), seed=1,
                                 noise_sigma=2.0)
    truth = seq.truth[0]
    gl = np.linalg.norm(truth.segments[:, 2:] - truth.segments[:, :2], axis=1)
    gt = truth.segments[(gl >= 40) & (truth.visible_fraction >= 0.9)]
    assert LineDetector().lsd_bins == 1024
    fine = LineDetector().detect(seq.frames[0])
    coarse = LineDetector(lsd_bins=32).detect(seq.frames[0])
    hit_fine, hit_coarse = _on_line(fine, gt), _on_line(coarse, gt)
    assert hit_coarse.mean() >= 0.9 and hit_coarse.sum() >= hit_fine.sum() - 2
    assert abs(len(coarse) - len(fine)) <= 0.1 * len(fine)


def test_callable_backend():
    fixed = np.array([[0, 0, 30, 0], [0, 0, 5, 0]], np.float32)
    det = LineDetector(backend=lambda g: fixed)
    out = det.detect(np.zeros((50, 50), np.uint8))
    np.testing.assert_allclose(out, fixed[:1])


def _hatched(seed, tilt_deg=7.0, cross_deg=38.0, stripe_px=3.0, period_px=10.0, size=160,
             stripes_from=-np.inf):
    """
    Cross-hatched face: a band 40 px wide, tilted, crossed by thin dark stripes.

    Stripes only right of column ``stripes_from`` px (default: everywhere on the face).

    Returns ``(image (size, size) uint8, band edge offsets (2,) px, unit normal (2,))``: the
    band's two edges are the lines ``(p - c) . normal = offset`` with ``c`` the image centre.
    Painted like the renderer's faces (albedo 150 x 1 / 0.3 stripes / 0.6 band / 0.12 both),
    supersampled 4x, sensor noise 2 grey levels.
    """
    ss = 4
    c = (np.arange(size * ss) + 0.5) / ss - 0.5
    y, x = np.meshgrid(c, c, indexing='ij')
    cx = (size - 1) / 2.0
    t = np.deg2rad(tilt_deg)
    normal = np.array([np.cos(t), np.sin(t)])
    across = (x - cx) * normal[0] + (y - cx) * normal[1]
    band = np.abs(across) <= 20.0
    a = t + np.deg2rad(90.0 - cross_deg)
    stripe = (np.mod((x - cx) * np.cos(a) + (y - cx) * np.sin(a), period_px) < stripe_px) \
        & (x >= stripes_from)
    face = (np.abs(x - cx) <= 60) & (np.abs(y - cx) <= 60)
    mult = np.where(stripe & band, 0.12, np.where(stripe, 0.3, np.where(band, 0.6, 1.0)))
    img = cv2.resize(np.where(face, 150.0 * mult, 70.0).astype(np.float32), (size, size),
                     interpolation=cv2.INTER_AREA)
    noisy = img + np.random.default_rng(seed).normal(0.0, 2.0, img.shape)
    return np.clip(np.rint(noisy), 0, 255).astype(np.uint8), np.array([-20.0, 20.0]), normal


def _longest_on(seg, offset, normal, centre, tol_px=1.0):
    """Length (px) of the longest segment within ``tol_px`` of the line, 0 if none."""
    o = (seg.reshape(-1, 2, 2) - centre) @ normal                       # (M, 2) offsets
    on = np.all(np.abs(o - offset) <= tol_px, axis=1)
    length = np.linalg.norm(seg[:, 2:] - seg[:, :2], axis=1)
    return float(length[on].max()) if on.any() else 0.0


@pytest.mark.parametrize('seed', [0, 1, 2])
def test_bridge_keeps_a_cross_hatched_band_edge_whole(seed):
    img, offsets, normal = _hatched(seed)
    centre = (img.shape[0] - 1) / 2.0
    # the stripes cross the band edges every ~16 px at 38 deg: LSD's support regions stop at
    # each crossing and are too small to report, so neither edge comes out of plain LSD
    plain = LineDetector(bridge=False).detect(img)
    assert all(_longest_on(plain, o, normal, centre) == 0.0 for o in offsets)
    seg = LineDetector(bridge=True).detect(img)
    for o in offsets:
        # each edge is one segment over (nearly) its whole 121 px inside the face
        assert _longest_on(seg, o, normal, centre) > 110.0, o
    # the stripes LSD found are kept as they were
    stripes = plain[np.linalg.norm(plain[:, 2:] - plain[:, :2], axis=1) > 30]
    assert _on_line(seg, stripes.astype(np.float64), dist_px=0.5).all()


@pytest.mark.parametrize('seed', [0, 1])
def test_bridge_leaves_reported_segments_as_they_are(seed):
    # stripes right of x = 100 only: LSD reports the lower band edge's clean left part, the
    # bridge finds its crossed right part
    img, offsets, normal = _hatched(seed, stripes_from=100.0)
    centre = (img.shape[0] - 1) / 2.0
    o = offsets[1]
    plain = LineDetector(bridge=False).detect(img)
    assert 40.0 < _longest_on(plain, o, normal, centre) < 70.0
    joined = LineDetector(bridge_join=True).detect(img)
    assert _longest_on(joined, o, normal, centre) > 110.0
    # default: a line that continues a reported segment is not added and the segment is kept
    # as reported (its extent is the tracker's business: growth, later detections)
    det = LineDetector()
    assert det.bridge and not det.bridge_join
    seg = det.detect(img)
    assert _longest_on(seg, o, normal, centre) == _longest_on(plain, o, normal, centre)
    np.testing.assert_array_equal(seg[:plain.shape[0]], plain)


def test_bridge_adds_nothing_without_crossings():
    # one stripe direction only (no crossings): the bridged detector changes nothing
    img = np.full((160, 160), 70, np.uint8)
    for k in range(5):
        cv2.line(img, (20, 30 + 25 * k), (140, 50 + 25 * k), 190, 6, cv2.LINE_AA)
    noisy = img + np.random.default_rng(3).normal(0.0, 2.0, img.shape)
    img = np.clip(np.rint(noisy), 0, 255).astype(np.uint8)
    np.testing.assert_array_equal(LineDetector(bridge=True).detect(img),
                                  LineDetector(bridge=False).detect(img))
    assert bridge_crossings(img, np.zeros((0, 4), np.float32)).shape == (0, 4)


def test_bridge_reuses_its_buffers_with_the_same_result():
    # the scratch dict only keeps whole-image buffers between calls: the lines found are the
    # same as with fresh buffers, also when the image size changes between calls
    scratch = {}
    for seed, size in ((0, 200), (1, 200), (2, 160), (0, 200)):
        img, _, _ = _hatched(seed, size=size)
        seg = LineDetector(bridge=False).detect(img)
        fresh = bridge_crossings(img, seg)
        assert fresh.shape[0] >= 2
        np.testing.assert_array_equal(bridge_crossings(img, seg, scratch=scratch), fresh)
        assert scratch['gx'].shape == img.shape


def test_bridge_sort_key_orders_each_hough_line_like_lexsort():
    # bridge_crossings sorts the pixels of every candidate line by one combined key
    # (line * span + position along it), unstable: right only if no two pixels of a line share
    # a position. The bins' normal angles ((i + 0.5) x 3 deg) have irrational slopes, so over a
    # whole 640x480 image the positions of distinct pixels differ by far more than the key's
    # rounding (< 1e-9 px for thousands of lines x span), and the order is lexsort's
    centre = (np.arange(HOUGH_BINS) + 0.5) * (np.pi / HOUGH_BINS)
    ys, xs = np.mgrid[0:480, 0:640]
    xs, ys = xs.ravel().astype(np.float64), ys.ravel().astype(np.float64)
    gaps = [np.diff(np.sort(ys * np.cos(a) - xs * np.sin(a))).min() for a in centre]
    assert min(gaps) > 1e-5
    rng = np.random.default_rng(0)
    pick = rng.integers(0, xs.size, 20000)
    c = rng.integers(0, HOUGH_BINS, pick.size)
    keep = np.unique(np.stack([c, pick]), axis=1)          # a pixel at most once per line
    c, px, py = keep[0], xs[keep[1]], ys[keep[1]]
    t = py * np.cos(centre[c]) - px * np.sin(centre[c])
    span = 4.0 * (int(np.ceil(np.hypot(480, 640))) + 2)
    np.testing.assert_array_equal(np.argsort(c * span + t), np.lexsort((t, c)))


def test_rows_not_in_matches_the_dense_comparison():
    # rows equal within the tolerance per coordinate, found by a sorted search on the first
    # coordinate: the same answer as comparing every row with every row
    rng = np.random.default_rng(5)
    base = np.round(rng.random((150, 4)) * 50.0).astype(np.float32)   # many ties in u1
    seg = np.concatenate([base[rng.permutation(150)[:60]],
                          base[:40] + rng.choice([-2e-3, -5e-4, 5e-4, 2e-3], (40, 4)),
                          np.round(rng.random((50, 4)) * 50.0)]).astype(np.float32)
    dense = ~(np.abs(seg[:, None] - base[None]).max(axis=2) <= 1e-3).any(axis=1)
    np.testing.assert_array_equal(rows_not_in(seg, base), dense)
    assert 0 < dense.sum() < seg.shape[0]
    assert rows_not_in(seg, base[:0]).all() and rows_not_in(seg[:0], base).shape == (0,)


def _bars():
    """Paint a 640x480 image: a horizontal bar across the middle, a small square at the left."""
    img = np.full((480, 640), 60, np.uint8)
    cv2.rectangle(img, (100, 200), (540, 260), 200, -1)       # edges v = 200 and 260
    cv2.rectangle(img, (20, 20), (80, 80), 200, -1)
    return np.clip(img + np.random.default_rng(0).normal(0, 2, img.shape), 0, 255
                   ).astype(np.uint8)


def test_detect_regions_finds_what_the_whole_image_finds_inside_a_box():
    det = LineDetector()
    img = _bars()
    full = det.detect(img)
    seg, clipped = det.detect_regions(img, np.array([[0, 0, 120, 120]]))
    # the square's four edges, at the whole image's coordinates
    assert len(seg) == 4 and not clipped.any()
    inside = full[(full[:, [0, 2]].max(axis=1) < 120) & (full[:, [1, 3]].max(axis=1) < 120)]
    assert len(inside) == 4
    for s in seg:
        d = np.abs(inside - s).max(axis=1)
        d = np.minimum(d, np.abs(inside - s[[2, 3, 0, 1]]).max(axis=1))
        assert d.min() < 0.5


def test_detect_regions_marks_lines_the_crop_cuts():
    det = LineDetector()
    img = _bars()
    # the box cuts the bar's long edges at u = 300; the image border at u = 0 cuts nothing
    seg, clipped = det.detect_regions(img, np.array([[0, 150, 300, 320]]))
    long = np.hypot(seg[:, 2] - seg[:, 0], seg[:, 3] - seg[:, 1]) > 100
    assert long.sum() == 2 and clipped[long].all()
    assert np.all(seg[long][:, [0, 2]].max(axis=1) > 297)      # they end at the crop side
    assert not clipped[~long].any()                              # the bar's left end (u = 100)
    with pytest.raises(ValueError, match='boxes'):
        det.detect_regions(img, np.array([[0, 0, 700, 100]]))
    with pytest.raises(ValueError, match='boxes'):
        det.detect_regions(img, np.array([[50, 0, 50, 100]]))
    empty, cut = det.detect_regions(img, np.zeros((0, 4), int))
    assert empty.shape == (0, 4) and cut.shape == (0,)
