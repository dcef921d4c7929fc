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

"""Smoke test of ``python -m mlofc_tools.bench accuracy --quick`` and its outlier generator."""
import pathlib

import numpy as np
import pytest

from mlofc_tools.bench import accuracy
from mlofc_tools.synthetic import make_scene

SECTION_TITLES = (
    '## Goals',
    '## 1. Robust vs the floor',
    '## 2. Outliers',
    '## 3. Multi-frame',
    '## 4. Number of bodies',
    '## 5. Solver speed',
)


def test_quick_run_writes_every_section(tmp_path: pathlib.Path) -> None:
    assert accuracy.main(['--quick', '--out', str(tmp_path)]) == 0
    text = (tmp_path / 'accuracy.md').read_text()
    for title in SECTION_TITLES:
        assert title in text, f'{title!r} missing from accuracy.md'
    # every section names the command that reruns it
    assert text.count('Command: `python -m mlofc_tools.bench accuracy --sections') == 5
    for name in ('floor', 'outliers', 'frames', 'speed'):
        png = tmp_path / f'accuracy_{name}.png'
        assert png.is_file() and png.stat().st_size > 1000, png


@pytest.mark.parametrize('mix', accuracy.MIXES)
def test_add_outliers(mix: str) -> None:
    scene = make_scene(2, 20, n_frames=3, noise_px=1.0, seed=3)
    rng = np.random.default_rng(0)
    tracks, kind = accuracy.add_outliers(scene.tracks, 0.15, rng, mix)
    assert tracks.shape == scene.tracks.shape
    assert np.sum(kind > 0) == 6
    np.testing.assert_array_equal(tracks[kind == 0], scene.tracks[kind == 0])
    if mix != 'stitched':
        jit = kind == 1
        moved = np.hypot(*(tracks[jit] - scene.tracks[jit]).reshape(-1, 2).T)
        assert np.all((moved >= 10.0 - 1e-9) & (moved <= 30.0 + 1e-9))
    if mix != 'jitter':
        # every frame of a stitched track is that frame of some OTHER line of the scene
        for i in np.flatnonzero(kind == 2):
            for k in range(scene.n_frames):
                same = np.all(scene.tracks[:, k] == tracks[i, k], axis=1)
                assert same.any() and not same[i]
    with pytest.raises(ValueError):
        accuracy.add_outliers(scene.tracks, 0.15, rng, 'bogus')


def test_ratio_ci_is_paired_ratio_of_means() -> None:
    a = np.array([0.1, 0.2, 0.3, 0.0])
    b = np.array([0.2, 0.2, 0.2, 0.2])
    val, lo, hi = accuracy.ratio_ci(a, b)
    assert val == pytest.approx(0.75)
    assert lo <= val <= hi
    assert np.isnan(accuracy.ratio_ci(a, np.zeros(4))[0])
