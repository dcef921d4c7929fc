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
Fuzz segment_lines: any input gives a well-formed result or a ValueError, nothing else.

Budgets (>= 10,000 solver calls in all, well under a minute): malformed inputs of every kind
(2000 examples x 5 methods, ~9000 calls, fast: rejected by the argument checks), edge floats
anywhere (700), near-valid tracks with known intrinsics (500, the cheap methods), unknown focal
length (30, expensive) and the 'general' method (8 + 4 hand-made hopeless cases, seconds each).
Array contents come from a numpy generator seeded by hypothesis (fast), except the 'raw'
pattern where hypothesis draws every float itself (edge values).
"""
import warnings

from hypothesis import given, HealthCheck, settings, strategies as st
from hypothesis.extra import numpy as hnp
from mlofc_ros.solver import get_method, METHODS, segment_lines
import numpy as np
import pytest

CHEAP_METHODS = [m for m in METHODS if m != 'general']
FUZZ = {'deadline': None, 'database': None, 'print_blob': True,
        'suppress_health_check': [HealthCheck.too_slow, HealthCheck.data_too_large,
                                  HealthCheck.filter_too_much]}
EDGE = [0.0, -0.0, 1e-300, -1e-300, 1e-9, 1.0, 1e12, -1e12, 1e300, -1e300, 1.7e308, -1.7e308,
        5e-324, np.nan]
SIZE = (640.0, 480.0)


def rotation(w: np.ndarray) -> np.ndarray:
    """Rotation matrix of rotation vector ``w`` (3,) (Rodrigues)."""
    theta = float(np.linalg.norm(w))
    if theta < 1e-15:
        return np.eye(3)
    k = w / theta
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(theta) * kx + (1 - np.cos(theta)) * kx @ kx


def scene(rng: np.random.Generator, n: int, k: int, bodies: int, deg: float,
          same: bool, f: float = 500.0) -> np.ndarray:
    """(n, k, 4) tracks of lines on ``bodies`` bodies rotating about the camera centre."""
    bodies = max(bodies, 1)
    axes = rng.normal(size=(bodies, 3))
    axes /= np.maximum(np.linalg.norm(axes, axis=1, keepdims=True), 1e-12)
    omega = np.deg2rad(deg) * axes
    if same:
        omega[:] = omega[0]
    kinv = np.linalg.inv(np.array([[f, 0, SIZE[0] / 2], [0, f, SIZE[1] / 2], [0, 0, 1.0]]))
    uv = rng.uniform(0, 1, (n, 2, 2)) * SIZE
    pts = np.einsum('ij,nej->nei', kinv, np.concatenate([uv, np.ones((n, 2, 1))], axis=2))
    pts *= rng.uniform(3, 9, (n, 2, 1))
    body = rng.integers(0, bodies, n)
    out = np.empty((n, k, 4))
    for b in range(bodies):                       # a loop over bodies and frames, not lines
        idx = body == b
        for j in range(k):
            q = pts[idx] @ np.linalg.matrix_power(rotation(omega[b]), j).T
            q = q[..., :2] / q[..., 2:] * f + np.array(SIZE) / 2
            out[idx, j] = q.reshape(-1, 4)
    return out


@st.composite
def track_array(draw, n_max: int = 10, k_max: int = 4, k_min: int = 2, n_min: int = 0):
    """Near-valid (N, K, 4) tracks with NaN holes, degenerate and odd values."""
    n = draw(st.integers(n_min, n_max))
    k = draw(st.integers(k_min, k_max))
    rng = np.random.default_rng(draw(st.integers(0, 2 ** 32 - 1)))
    base = draw(st.sampled_from(['scene', 'scene', 'scene', 'same_motion', 'static', 'uniform',
                                 'zeros', 'constant', 'huge', 'tiny', 'integers', 'one_track',
                                 'collinear', 'raw']))
    if base == 'raw':
        floats = st.one_of(st.sampled_from(EDGE), st.floats(-1e4, 1e4))
        return draw(hnp.arrays(np.float64, (n, k, 4), elements=floats))
    if base in ('scene', 'same_motion', 'static'):
        deg = 0.0 if base == 'static' else draw(st.sampled_from([1e-6, 0.5, 3.0, 30.0, 179.0]))
        arr = scene(rng, n, k, draw(st.integers(1, 4)), deg, base == 'same_motion')
        arr += rng.normal(scale=draw(st.sampled_from([0.0, 0.5, 5.0])), size=arr.shape)
    elif base == 'uniform':
        arr = rng.uniform(-100, 800, (n, k, 4))
    elif base == 'zeros':
        arr = np.zeros((n, k, 4))
    elif base == 'constant':
        arr = np.full((n, k, 4), rng.uniform(-1e3, 1e3))
    elif base == 'huge':
        arr = rng.uniform(-1, 1, (n, k, 4)) * 10.0 ** rng.integers(6, 300)
    elif base == 'tiny':
        arr = rng.uniform(-1, 1, (n, k, 4)) * 10.0 ** -rng.integers(6, 300)
    elif base == 'integers':
        arr = rng.integers(0, 4, (n, k, 4)).astype(float)
    elif base == 'one_track':
        arr = np.broadcast_to(rng.uniform(0, 640, (1, k, 4)), (n, k, 4)).copy()
    else:                                          # all segments on one image line
        t = rng.uniform(0, 640, (n, k, 2))
        arr = np.stack([t[..., 0], 0.5 * t[..., 0] + 3, t[..., 1], 0.5 * t[..., 1] + 3], -1)
    if n and draw(st.booleans()):                  # NaN holes: coordinates, frames, tracks
        arr[rng.random(arr.shape) < draw(st.sampled_from([0.05, 0.3, 0.9]))] = np.nan
    if n and draw(st.booleans()):
        arr[rng.random((n, k)) < 0.3] = np.nan
    if n and draw(st.booleans()):                  # degenerate: both endpoints the same
        sel = rng.random((n, k)) < draw(st.sampled_from([0.2, 1.0]))
        arr[sel, 2:] = arr[sel, :2]
    if n and draw(st.booleans()):
        arr[rng.integers(0, n)] = np.nan           # a track with no frame at all
    return arr


@st.composite
def cheap_tracks(draw, n_max: int = 6, k_max: int = 3):
    """(N, K, 4) tracks from a seeded generator: few draws, so thousands of examples are cheap."""
    n, k, seed, kind = draw(st.tuples(st.integers(0, n_max), st.integers(2, k_max),
                                      st.integers(0, 2 ** 32 - 1), st.integers(0, 3)))
    rng = np.random.default_rng(seed)
    if kind == 0:
        arr = scene(rng, n, k, int(rng.integers(1, 4)), 3.0, False)
    elif kind == 1:
        arr = rng.uniform(-100, 800, (n, k, 4))
    else:
        arr = np.zeros((n, k, 4)) if kind == 2 else np.full((n, k, 4), 1e300)
    arr[rng.random(arr.shape) < 0.2 * rng.integers(0, 3)] = np.nan
    return arr


def good_intrinsics():
    return st.one_of(st.just((500.0, 500.0, 320.0, 240.0)),
                     st.tuples(st.floats(1e-3, 1e7), st.floats(1e-3, 1e7),
                               st.floats(-1e4, 1e4), st.floats(-1e4, 1e4)))


def any_intrinsics():
    value = st.one_of(st.sampled_from([0.0, -0.0, -1.0, -500.0, np.nan, np.inf, -np.inf, 1e-300,
                                       1e300, 500.0, 320.0]),
                      st.floats(allow_nan=True, allow_infinity=True))
    return st.one_of(st.none(), good_intrinsics(), st.tuples(value, value, value, value),
                     st.lists(value, min_size=0, max_size=6), value,
                     hnp.arrays(np.float64, st.sampled_from([(4,), (2, 2), (1, 4), (3,)]),
                                elements=value))


def any_image_size():
    value = st.one_of(st.sampled_from([0.0, -1.0, np.nan, np.inf, 1.0, 640.0]),
                      st.floats(allow_nan=True, allow_infinity=True))
    return st.one_of(st.none(), st.just(SIZE), st.tuples(value, value),
                     st.lists(value, min_size=0, max_size=3))


def init_labels(n: int):
    """None or (N,) labels from an earlier window: -1 unknown, maybe >= n_bodies, maybe < -1."""
    return st.one_of(st.none(), hnp.arrays(np.int64, (n,), elements=st.integers(-1, 6)),
                     hnp.arrays(np.int64, (n,), elements=st.integers(-3, 9)))


def check(tracks, n_bodies, intrinsics, image_size, method, seed=0, labels=None):
    """Run the solver; a ValueError is fine, a result must be well formed, the rest fails."""
    with warnings.catch_warnings():
        warnings.simplefilter('ignore')
        try:
            res = segment_lines(tracks, n_bodies, intrinsics=intrinsics, image_size=image_size,
                                method=method, seed=seed, init_labels=labels)
        except ValueError:
            return None
    n_tracks = np.asarray(tracks).shape[0]
    lab = np.asarray(res.labels)
    nb = res.angular_velocities.shape[0]
    assert lab.shape == (n_tracks,) and lab.dtype.kind == 'i', lab
    assert np.all((lab >= -1) & (lab < nb)), (lab, nb)
    if n_bodies > 0:
        assert nb == n_bodies, (nb, n_bodies)
    assert res.angular_velocities.shape == (nb, 3)
    assert res.angular_covariances.shape == (nb, 3, 3)
    assert np.asarray(res.residuals).shape == (n_tracks,)
    return res


# --- malformed: every example has at least one defect the argument checks must catch -------


@st.composite
def malformed(draw):
    defect = draw(st.sampled_from(['shape', 'inf', 'intrinsics', 'image_size', 'n_bodies',
                                   'method', 'too_few', 'not_numeric']))
    method = draw(st.sampled_from(METHODS))
    n_bodies = draw(st.integers(1, 5))
    intr = draw(st.one_of(st.none(), good_intrinsics()))
    size = SIZE
    tracks = draw(cheap_tracks())
    if defect == 'shape':
        shape = draw(st.one_of(
            st.tuples(st.integers(0, 4), st.integers(0, 1), st.just(4)),
            st.tuples(st.integers(0, 4), st.integers(0, 3), st.integers(0, 8).filter(
                lambda c: c != 4)),
            st.lists(st.integers(0, 3), min_size=0, max_size=5).filter(lambda s: len(s) != 3)))
        tracks = np.random.default_rng(len(shape)).uniform(0, 640, tuple(shape))
        if draw(st.booleans()):
            tracks = tracks.tolist()
    elif defect == 'inf':
        if tracks.size == 0:
            tracks = np.zeros((1, 2, 4))
        flat = tracks.reshape(-1)
        flat[draw(st.integers(0, flat.size - 1))] = draw(st.sampled_from([np.inf, -np.inf]))
    elif defect == 'intrinsics':
        bad = draw(st.sampled_from([0.0, -1.0, np.nan, np.inf, -np.inf]))
        where = draw(st.integers(0, 3))
        vals = list(draw(good_intrinsics()))
        vals[where] = bad if where < 2 or not np.isfinite(bad) else np.nan
        intr = draw(st.sampled_from([tuple(vals), vals[:draw(st.integers(0, 3))],
                                     vals + [1.0], np.array(vals)]))
    elif defect == 'image_size':
        intr = None
        size = draw(st.one_of(st.none(), st.tuples(st.sampled_from([0.0, -5.0, np.nan, np.inf]),
                                                   st.floats(1, 1e4)),
                              st.lists(st.floats(1, 1e4), min_size=0, max_size=1),
                              st.lists(st.floats(1, 1e4), min_size=3, max_size=4)))
    elif defect == 'n_bodies':
        n_bodies = draw(st.sampled_from([-1, -5, 1.5, 0.5, -0.5, np.nan, np.float64(2.2), '2',
                                         'two', True, False]))
    elif defect == 'method':
        method = draw(st.sampled_from(['', 'ROBUST', 'robust ', 'gpca', 'ransac', None, 3]))
    elif defect == 'too_few':
        intr = draw(good_intrinsics())
        n_bodies = draw(st.integers(2, 5))
        tracks = draw(cheap_tracks(n_max=2 * n_bodies - 1))
    else:
        tracks = draw(st.sampled_from(['abc', None, [[[1, 2, 3, 'x']] * 2], {'a': 1},
                                       [[[1, 2, 3, 4], [1, 2]]], object(), [[[1j, 2, 3, 4]] * 2]]))
    return tracks, n_bodies, intr, size, method, defect


@settings(max_examples=2000, **FUZZ)
@given(malformed(), st.integers(0, 2 ** 31 - 1))
def test_malformed_inputs_raise_value_error(case, seed):
    """2000 examples, each under every method (5 calls) unless the method is the defect."""
    tracks, n_bodies, intr, size, method, defect = case
    for m in METHODS if defect != 'method' else [method]:
        res = check(tracks, n_bodies, intr, size, m, seed)
        assert res is None, f'{defect} was accepted by {m}'


# --- near valid ------------------------------------------------------------------------------


@st.composite
def near_valid(draw, methods, intrinsics, n_max=10, k_max=4):
    tracks = draw(track_array(n_max=n_max, k_max=k_max))
    n_bodies = draw(st.integers(-1, 5))
    return (tracks, n_bodies, draw(intrinsics), draw(any_image_size()),
            draw(st.sampled_from(methods)), draw(st.integers(0, 2 ** 31 - 1)),
            draw(init_labels(len(tracks))))


@settings(max_examples=500, **FUZZ)
@given(near_valid(CHEAP_METHODS, st.one_of(good_intrinsics(), any_intrinsics())))
def test_near_valid_tracks_known_focal(case):
    tracks, n_bodies, intr, size, method, seed, labels = case
    if n_bodies == 0 and len(tracks) > 6:
        n_bodies = 1                     # model selection runs every n: keep it for small N
    check(tracks, n_bodies, intr, size, method, seed, labels)


@settings(max_examples=30, **FUZZ)
@given(near_valid(CHEAP_METHODS, st.none(), n_max=8, k_max=3))
def test_near_valid_tracks_unknown_focal(case):
    tracks, n_bodies, intr, size, method, seed, labels = case
    check(tracks, n_bodies, None, SIZE if size is None else size, method, seed, labels)


@settings(max_examples=8, **FUZZ)
@given(track_array(n_min=4, n_max=6, k_min=3, k_max=3), st.integers(1, 2),
       st.one_of(good_intrinsics(), st.none()), st.integers(0, 2 ** 31 - 1))
def test_general_method(tracks, n_bodies, intr, seed):
    """Few examples (seconds each): three frames, so the general model really runs."""
    check(tracks, n_bodies, intr, SIZE, 'general', seed)


def test_general_method_on_hopeless_inputs():
    """Bodies alike, no motion, one track repeated, all NaN but one frame: no crash."""
    rng = np.random.default_rng(3)
    alike = scene(rng, 6, 3, 2, 3.0, True)
    one_frame = scene(rng, 6, 3, 2, 3.0, False)
    one_frame[:, 1:] = np.nan
    cases = [(alike, 3), (scene(rng, 6, 3, 1, 0.0, False), 2),
             (np.repeat(scene(rng, 1, 3, 1, 3.0, False), 6, axis=0), 2), (one_frame, 1)]
    for tracks, n_bodies in cases:
        check(tracks, n_bodies, (500.0, 500.0, 320.0, 240.0), SIZE, 'general', 0)


@settings(max_examples=700, **FUZZ)
@given(hnp.arrays(np.float64, st.tuples(st.integers(0, 5), st.integers(2, 3), st.just(4)),
                  elements=st.one_of(st.sampled_from(EDGE), st.floats())),
       st.integers(-1, 3), any_intrinsics(), any_image_size(), st.sampled_from(CHEAP_METHODS))
def test_edge_floats_anywhere(tracks, n_bodies, intr, size, method):
    check(tracks, n_bodies, intr, size, method)


@pytest.mark.parametrize('method', [m for m in METHODS if get_method(m).accepts('init_labels')])
def test_init_labels_of_the_wrong_length_are_a_value_error(method):
    tracks = scene(np.random.default_rng(0), 6, 3, 2, 3.0, False)
    intr = (500.0, 500.0, 320.0, 240.0)
    right = segment_lines(tracks, 1, intr, SIZE, method, init_labels=np.zeros(6, np.int64))
    assert right.labels.shape == (6,)
    for labels in (np.zeros(1, np.int64), np.zeros(7, np.int64), np.zeros((6, 2), np.int64)):
        with pytest.raises(ValueError, match=r'init_labels must have shape \(6,\)'):
            segment_lines(tracks, 1, intr, SIZE, method, init_labels=labels)
