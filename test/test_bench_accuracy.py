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

"""Smoke test of ``python -m mlofc_tools.bench accuracy --quick`` and its statistics."""
import pathlib

from mlofc_tools.bench import accuracy, accuracy_report
import numpy as np
import pytest

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
    text = (tmp_path / 'README.md').read_text()
    for title in SECTION_TITLES:
        assert title in text, f'{title!r} missing from the report'
    # every section names the command that reruns it
    assert text.count('Command: `python -m mlofc_tools.bench accuracy --sections') == 5
    for name in ('floor', 'outliers', 'frames', 'speed'):
        png = tmp_path / f'accuracy_{name}.png'
        assert png.is_file() and png.stat().st_size > 1000, png


def test_ratio_ci_is_paired_ratio_of_means() -> None:
    a = np.array([0.1, 0.2, 0.3, 0.0])
    b = np.array([0.2, 0.2, 0.2, 0.2])
    val, lo, hi = accuracy_report.ratio_ci(a, b)
    assert val == pytest.approx(0.75)
    assert lo <= val <= hi
    assert np.isnan(accuracy_report.ratio_ci(a, np.zeros(4))[0])
